//! `--capture FILE` end to end: a `robobus wck` command against `robobus sim wck` (its own
//! process, on a pty) records what it wrote and read, and `robobus replay` decodes the file
//! with the command and reply it carried; an existing capture file is never overwritten and
//! nothing is sent then.
#![cfg(target_os = "linux")]
#![allow(clippy::unwrap_used, clippy::panic)] // test helpers: a failed unwrap is a failed test

use crate::common;

use common::robobus;

#[test]
fn wck_capture_replays_as_the_command_and_its_reply() {
    let dir = tempfile::tempdir().unwrap();
    let sim_file = dir.path().join("sim.log");
    let sim = common::WckSim::start("0-2", &["--capture", sim_file.to_str().unwrap()]);
    let file = dir.path().join("wck.log");
    let file = file.to_str().unwrap();
    let wck = |extra: &[&str]| {
        let mut args = vec!["wck", "--port", sim.port(), "--reply-margin", "300"];
        args.extend_from_slice(extra);
        robobus(&args)
    };
    let r = wck(&["--capture", file, "move", "2", "200"]);
    assert_eq!(r.code, Some(0), "{r:#?}");
    let r = robobus(&["replay", file]);
    assert_eq!(r.code, Some(0), "{r:#?}");
    let lines: Vec<&str> = r.stdout.lines().collect();
    // FF, torque 0 / ID 2 = 0x02, target 200 = 0xC8, checksum (0x02 ^ 0xC8) & 0x7F = 0x4A.
    assert!(
        lines[0].ends_with(" > FF 02 C8 4A  position move servo 2 to 200 (torque 0)"),
        "{lines:?}"
    );
    // The reply carries the load and the position before the move (the servo stood at 127).
    assert!(
        lines[1].ends_with(" < 00 7F  load 0, position 127"),
        "{lines:?}"
    );
    assert_eq!(
        lines.last().copied(),
        Some("# 2 entries: 1 requests, 1 replies, 0 missing replies, 0 unexpected, 0 malformed")
    );
    // The simulator's own capture: the packet it read (`<`) and the reply it wrote (`>`),
    // which the replay shows the host's way round, with the same meanings.
    let raw = std::fs::read_to_string(&sim_file).unwrap();
    let raw: Vec<&str> = raw.lines().collect();
    assert!(raw[0].contains("device side"), "{raw:?}");
    // The simulated wire releases each reply byte when its last bit is sent, so the reply
    // may be logged in one write or two.
    assert!(raw[1].ends_with(" < FF 02 C8 4A"), "{raw:?}");
    let written: Vec<&str> = raw[2..]
        .iter()
        .filter_map(|l| l.split_once(" > ").map(|(_, hex)| hex))
        .collect();
    assert_eq!(written.join(" "), "00 7F", "{raw:?}");
    let r = robobus(&["replay", sim_file.to_str().unwrap()]);
    assert_eq!(r.code, Some(0), "{r:#?}");
    let lines: Vec<&str> = r.stdout.lines().collect();
    assert!(
        lines[0].ends_with(" > FF 02 C8 4A  position move servo 2 to 200 (torque 0)"),
        "{lines:?}"
    );
    assert!(
        lines[1].ends_with(" < 00 7F  load 0, position 127"),
        "{lines:?}"
    );
    // The file exists now: a second capture into it is refused before anything is sent.
    let before = std::fs::read_to_string(file).unwrap();
    let r = wck(&["--capture", file, "move", "2", "50"]);
    assert_eq!(r.code, Some(2), "{r:#?}");
    assert!(r.stderr.contains("already exists"), "{r:#?}");
    assert_eq!(std::fs::read_to_string(file).unwrap(), before);
}
