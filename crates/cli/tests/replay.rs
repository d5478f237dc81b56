//! `robobus replay FILE`: a capture file decoded end to end by the built binary (text,
//! `--json`, `--strict`), bad files refused with exit code 2 naming the file and line.

#![allow(clippy::unwrap_used, clippy::panic)] // test helpers: a failed unwrap is a failed test

use crate::common;

use std::fmt::Write as _;
use std::path::PathBuf;

use common::robobus;

const WCK_LOG: &str = "\
# robobus hex capture: host side (> host wrote, < host read)
0.000100 > FF A3 00 23
0.000900 < 00 7F
0.001000 > FF A5 00 25
0.012000 > FF A3 00 22
0.013000 < 7F
";

const WHJ_LOG: &str = "\
(1795360410.000100) can0 001##5020A01
(1795360410.000300) can0 101##5020A01
(1795360410.000500) can0 501##5F4010000E8030000A086010001000208
this is not a frame
";

fn write(dir: &tempfile::TempDir, name: &str, text: &str) -> PathBuf {
    let p = dir.path().join(name);
    std::fs::write(&p, text).unwrap();
    p
}

#[test]
fn replay_prints_one_line_per_packet_and_reply() {
    let dir = tempfile::tempdir().unwrap();
    let p = write(&dir, "wck.log", WCK_LOG);
    let r = robobus(&["replay", p.to_str().unwrap()]);
    assert_eq!(r.code, Some(0), "{r:#?}");
    assert_eq!(
        r.stdout,
        "\
0.000100 > FF A3 00 23  status read servo 3
0.000900 < 00 7F  load 0, position 127
0.001000 > FF A5 00 25  status read servo 5
0.001000 <  NO REPLY to status read (none before the next packet (line 5))
0.012000 > FF A3 00 22  MALFORMED: bad checksum: computed 0x23, received 0x22 (line 5)
0.013000 < 7F  UNEXPECTED: no command was waiting for a reply (line 6)
# 6 entries: 2 requests, 1 replies, 1 missing replies, 1 unexpected, 1 malformed
"
    );
    let p = write(&dir, "whj.log", WHJ_LOG);
    let r = robobus(&["replay", p.to_str().unwrap()]);
    assert_eq!(r.code, Some(0), "{r:#?}");
    assert_eq!(
        r.stdout,
        "\
1795360410.000100 > 001 02 0A 01  J1 write SYS_ENABLE_DRIVER 1
1795360410.000300 < 101 02 0A 01  J1 write ack SYS_ENABLE_DRIVER: ok
1795360410.000500 < 501 F4 01 00 00 E8 03 00 00 A0 86 01 00 01 00 02 08  UNEXPECTED: no request to this joint was waiting for it: J1 servo feedback: position 10.0000 °, speed 20.00 RPM, current 500 mA, enabled, errors: over-voltage, following error (line 3)
- ?  MALFORMED: expected `(seconds.micros) iface ID#data`: \"this is not a frame\" (line 4)
# 4 entries: 1 requests, 1 replies, 0 missing replies, 1 unexpected, 1 malformed
"
    );
    // Joint 60 / 120: 2 mA per count.
    let r = robobus(&["replay", "--current-scale", "2", p.to_str().unwrap()]);
    assert!(r.stdout.contains("current 1000 mA"), "{r:#?}");
}

#[test]
fn replay_json_is_one_document_with_the_typed_entries() {
    let dir = tempfile::tempdir().unwrap();
    let p = write(&dir, "whj.log", WHJ_LOG);
    let r = robobus(&["replay", "--json", p.to_str().unwrap()]);
    assert_eq!(r.code, Some(0), "{r:#?}");
    let doc: serde_json::Value = serde_json::from_str(&r.stdout).unwrap();
    assert_eq!(doc["format"], "candump");
    assert_eq!(doc["side"], serde_json::Value::Null);
    assert_eq!(doc["summary"]["entries"], 4);
    assert_eq!(doc["summary"]["malformed"], 1);
    let fb = &doc["entries"][2];
    assert_eq!(fb["can_id"], 0x501);
    assert_eq!(fb["direction"], "from-device");
    assert_eq!(fb["device"], 1);
    assert_eq!(fb["command"], "servo feedback");
    assert_eq!(fb["fields"][0]["name"], "position");
    assert_eq!(fb["fields"][0]["raw"], 100_000);
    assert_eq!(fb["fields"][0]["unit"], "°");
    assert_eq!(fb["fields"][2]["value"], 500.0);
    assert_eq!(
        fb["errors"],
        serde_json::json!(["over-voltage", "following error"])
    );
    assert_eq!(doc["entries"][3]["kind"], "malformed");
    assert_eq!(doc["entries"][3]["line"], 4);
    let p = write(&dir, "wck.log", WCK_LOG);
    let r = robobus(&["replay", "--json", p.to_str().unwrap()]);
    let doc: serde_json::Value = serde_json::from_str(&r.stdout).unwrap();
    assert_eq!(doc["side"], "host");
    assert_eq!(doc["entries"][1]["fields"][1]["name"], "position");
    assert_eq!(doc["entries"][1]["fields"][1]["raw"], 127);
}

#[test]
fn bad_files_exit_2_naming_the_file_and_line() {
    let dir = tempfile::tempdir().unwrap();
    let missing = dir.path().join("none.log");
    let r = robobus(&["replay", missing.to_str().unwrap()]);
    assert_eq!(r.code, Some(2), "{r:#?}");
    assert!(r.stderr.contains("none.log: cannot open"), "{}", r.stderr);
    let p = write(&dir, "junk.log", "\n\nhello world\n");
    let r = robobus(&["replay", p.to_str().unwrap()]);
    assert_eq!(r.code, Some(2), "{r:#?}");
    assert!(
        r.stderr
            .contains("junk.log: line 3: neither a candump log line"),
        "{}",
        r.stderr
    );
    assert!(r.stdout.is_empty());
    let p = dir.path().join("bin.log");
    std::fs::write(&p, b"0.1 > FF\n\xC3\x28\n").unwrap();
    let r = robobus(&["replay", p.to_str().unwrap()]);
    assert_eq!(r.code, Some(2), "{r:#?}");
    assert!(
        r.stderr.contains("bin.log: line 2: not UTF-8 text"),
        "{}",
        r.stderr
    );
    // --strict stops at the first malformed entry, naming its line.
    let p = write(&dir, "whj.log", WHJ_LOG);
    let r = robobus(&["replay", "--strict", p.to_str().unwrap()]);
    assert_eq!(r.code, Some(2), "{r:#?}");
    assert!(
        r.stderr
            .contains("whj.log: line 4: malformed: expected `(seconds.micros)"),
        "{}",
        r.stderr
    );
    let r = robobus(&["replay", "--current-scale", "3", p.to_str().unwrap()]);
    assert_eq!(r.code, Some(2), "{r:#?}");
    assert!(r.stderr.contains("--current-scale"), "{}", r.stderr);
}

#[test]
fn replay_help_matches_its_snapshot() {
    let r = robobus(&["replay", "--help"]);
    assert_eq!(r.code, Some(0));
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/snapshots/help-replay.txt");
    if std::env::var_os("UPDATE_SNAPSHOTS").is_some_and(|v| v == "1") {
        std::fs::write(&path, &r.stdout).unwrap();
    }
    assert_eq!(std::fs::read_to_string(&path).unwrap(), r.stdout);
}

#[test]
fn a_byte_order_mark_a_symlink_loop_and_a_closed_pipe_are_handled() {
    let dir = tempfile::tempdir().unwrap();
    // A UTF-8 byte-order mark before the first line is not part of the capture.
    let p = dir.path().join("bom.log");
    std::fs::write(&p, b"\xEF\xBB\xBF(100.000001) can0 601##1\n").unwrap();
    let r = robobus(&["replay", p.to_str().unwrap()]);
    assert_eq!(r.code, Some(0), "{r:#?}");
    assert!(r.stdout.contains("J1 status query"), "{r:#?}");
    // A symlink loop is a path that cannot be a file: bad input, exit 2 (Unix: making a
    // symbolic link on Windows needs a privilege).
    #[cfg(unix)]
    {
        let (a, b) = (dir.path().join("a"), dir.path().join("b"));
        std::os::unix::fs::symlink(&b, &a).unwrap();
        std::os::unix::fs::symlink(&a, &b).unwrap();
        let r = robobus(&["replay", a.to_str().unwrap()]);
        assert_eq!(r.code, Some(2), "{r:#?}");
        assert!(r.stderr.contains("symbolic links"), "{r:#?}");
    }
    // A reader that stops reading (`| head`) ends the replay quietly.
    let big = dir.path().join("big.log");
    let mut text = String::new();
    for i in 1..=20_000 {
        writeln!(text, "(100.{i:06}) can0 601##1").unwrap();
    }
    std::fs::write(&big, text).unwrap();
    let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_robobus"))
        .args(["replay", big.to_str().unwrap()])
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let mut line = String::new();
    let mut out = std::io::BufReader::new(child.stdout.take().unwrap());
    std::io::BufRead::read_line(&mut out, &mut line).unwrap();
    drop(out);
    let done = child.wait_with_output().unwrap();
    assert!(line.contains("J1 status query"), "{line}");
    assert_eq!(done.status.code(), Some(0), "{done:?}");
    assert!(
        done.stderr.is_empty(),
        "{}",
        String::from_utf8_lossy(&done.stderr)
    );
}
