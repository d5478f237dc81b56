//! End to end: the built `robobus wck ...` against `robobus sim wck` running as a separate
//! process on a pseudo-terminal (the way a user runs them), for every wCK subcommand: the
//! tables, the JSON documents, the effects on the simulated servos (read back through the
//! CLI itself), bad input and the exit codes.
#![cfg(target_os = "linux")]
#![allow(clippy::unwrap_used, clippy::panic)] // test helpers: a failed unwrap is a failed test

use crate::common;

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use common::{Run, robobus};
use serde_json::Value;

/// `--reply-margin` for the clients, in ms: the simulator is another process on the wall
/// clock, and a shared virtual machine stalls processes for up to ~200 ms; a reply that
/// misses its deadline would be taken for the next command's (wCK replies carry no ID).
const MARGIN: &str = "300";

/// Sends SIGINT (Ctrl-C) to `child` and waits for it to end.
fn interrupt(child: std::process::Child) -> std::process::Output {
    let signalled = Command::new("kill")
        .arg("-INT")
        .arg(child.id().to_string())
        .status()
        .unwrap();
    assert!(signalled.success());
    child.wait_with_output().unwrap()
}

/// `robobus sim wck` in its own process, driven through `robobus wck`.
struct Sim(common::WckSim);

impl Sim {
    /// Starts a simulated bus with `servos` (e.g. `0-2`) and waits until it is up.
    fn start(servos: &str, extra: &[&str]) -> Self {
        Self(common::WckSim::start(servos, extra))
    }

    fn port(&self) -> &str {
        self.0.port()
    }

    /// `robobus wck --port LINK --reply-margin MARGIN ARGS`.
    fn wck(&self, args: &[&str]) -> Run {
        let mut all = vec!["wck", "--port", self.port(), "--reply-margin", MARGIN];
        all.extend_from_slice(args);
        robobus(&all)
    }

    /// Like [`Sim::wck`] and requires exit code 0; returns stdout.
    #[track_caller]
    fn ok(&self, args: &[&str]) -> String {
        let r = self.wck(args);
        assert_eq!(r.code, Some(0), "wck {args:?}: {r:#?}");
        r.stdout
    }

    /// `--json` run, exit 0, parsed.
    #[track_caller]
    fn json(&self, args: &[&str]) -> Value {
        let mut all = vec!["--json"];
        all.extend_from_slice(args);
        serde_json::from_str(&self.ok(&all)).unwrap()
    }

    /// The first result of a `--json` run.
    #[track_caller]
    fn result(&self, args: &[&str]) -> Value {
        let v = self.json(args);
        v["results"][0].clone()
    }

    /// The position servo `id` reports.
    #[track_caller]
    fn position(&self, id: u8) -> u64 {
        self.result(&["status", &id.to_string()])["position"]
            .as_u64()
            .unwrap()
    }

    /// Polls the position of `id` until two reads 150 ms apart differ by at most a step
    /// (3 s at most); the position it came to rest at.
    #[track_caller]
    fn at_rest(&self, id: u8) -> u64 {
        let resting = Instant::now();
        let mut stopped = self.position(id);
        loop {
            std::thread::sleep(Duration::from_millis(150));
            let p = self.position(id);
            if p.abs_diff(stopped) <= 1 {
                return stopped;
            }
            stopped = p;
            assert!(
                resting.elapsed() < Duration::from_secs(3),
                "servo {id} never came to rest"
            );
        }
    }

    /// Polls the position of `id` until it is within 3 steps of `target` (3 s at most;
    /// the simulated shaft settles within the controller's dead band).
    #[track_caller]
    fn wait_at(&self, id: u8, target: u64) {
        let deadline = Instant::now() + Duration::from_secs(3);
        loop {
            let p = self.position(id);
            if p.abs_diff(target) <= 3 {
                return;
            }
            assert!(
                Instant::now() < deadline,
                "servo {id} stays at {p}, expected {target}"
            );
            std::thread::sleep(Duration::from_millis(50));
        }
    }
}

fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p
}

#[test]
fn status_move_and_10_bit_moves_show_their_effect() {
    let sim = Sim::start("0-2", &[]);
    // A table with a header and one row per servo, at the factory position 127.
    let out = sim.ok(&["status", "0-2"]);
    let lines: Vec<&str> = out.lines().collect();
    assert_eq!(lines.len(), 4, "{out}");
    assert!(
        lines[0].starts_with("ID") && lines[0].contains("POSITION"),
        "{out}"
    );
    for (i, l) in lines[1..].iter().enumerate() {
        let cells: Vec<&str> = l.split_whitespace().collect();
        assert_eq!(cells[0], i.to_string(), "{out}");
        assert_eq!(cells[2], "127", "{out}");
    }
    // JSON: stable fields with units in their names.
    let v = sim.json(&["status", "1"]);
    assert_eq!(v["op"], "wck.status");
    assert_eq!(v["bus"], sim.port());
    let r = &v["results"][0];
    assert_eq!(r["id"], 1);
    assert_eq!(r["position"], 127);
    assert!(
        (r["degrees"].as_f64().unwrap() - 133.97).abs() < 0.01,
        "{r}"
    );
    assert!(r["load"].is_u64(), "{r}");

    // A move replies the status before it; status shows where it went.
    let m = sim.result(&["move", "1", "200", "--torque", "1"]);
    assert_eq!(m["target_position"], 200);
    assert_eq!(m["position_before"], 127);
    assert_eq!(m["torque"], 1);
    sim.wait_at(1, 200);
    assert_eq!(sim.position(0), 127, "servo 0 did not move");

    // 10-bit read and move.
    let r = sim.result(&["read10", "2"]);
    let p10 = r["position10"].as_u64().unwrap();
    assert!(p10.abs_diff(412) <= 3, "{r}");
    let m = sim.result(&["move10", "2", "600"]);
    assert_eq!(m["target_position10"], 600);
    assert_eq!(m["position10_before"], p10);
    let deadline = Instant::now() + Duration::from_secs(3);
    loop {
        let p = sim.result(&["read10", "2"])["position10"].as_u64().unwrap();
        if p.abs_diff(600) <= 4 {
            break;
        }
        assert!(Instant::now() < deadline, "10-bit move ends at {p}");
        std::thread::sleep(Duration::from_millis(50));
    }

    // Bad input: exit 2 before anything is sent (servo 0 stays where it is).
    let r = sim.wck(&["move", "0", "255"]);
    assert_eq!(r.code, Some(2), "{r:#?}");
    assert!(
        r.stderr.contains("255") && r.stderr.contains("0..=254"),
        "{}",
        r.stderr
    );
    let r = sim.wck(&["move", "31", "100"]);
    assert_eq!(r.code, Some(2), "{r:#?}");
    assert_eq!(sim.position(0), 127);
}

#[test]
fn a_servo_that_does_not_answer_is_exit_3_naming_the_port_and_the_servo() {
    let sim = Sim::start("0-1", &[]);
    let r = sim.wck(&["status", "9"]);
    assert_eq!(r.code, Some(3), "{r:#?}");
    assert!(r.stderr.contains(sim.port()), "{}", r.stderr);
    assert!(r.stderr.contains("servo 9"), "{}", r.stderr);
    // Every servo has its row, the silent one marked as such, then the error.
    let r = sim.wck(&["status", "0-2"]);
    assert_eq!(r.code, Some(3), "{r:#?}");
    assert!(r.stderr.contains("servo 2"), "{}", r.stderr);
    let lines: Vec<&str> = r.stdout.lines().collect();
    assert_eq!(lines.len(), 4, "{}", r.stdout);
    assert!(
        lines[3].starts_with("2 ") && lines[3].contains("no-device"),
        "{}",
        r.stdout
    );
    assert!(!lines[1].contains("no-device"), "{}", r.stdout);
    // A silent servo does not hide the ones after it.
    let r = sim.wck(&["status", "2,0,1"]);
    assert_eq!(r.code, Some(3), "{r:#?}");
    let lines: Vec<&str> = r.stdout.lines().collect();
    assert_eq!(lines.len(), 4, "servos 0 and 1 are shown: {}", r.stdout);
    assert!(lines[1].contains("no-device"), "{}", r.stdout);
    assert!(
        lines[2].contains(" 127 ") && lines[3].contains(" 127 "),
        "{}",
        r.stdout
    );
    assert!(r.stderr.contains("servo 2"), "{}", r.stderr);
    let v: Value = serde_json::from_str(&sim.wck(&["--json", "status", "2,0,1"]).stdout).unwrap();
    assert_eq!(v["results"][0]["kind"], "no-device", "{v}");
    assert_eq!(v["results"][1]["position"], 127, "{v}");
    // Spinning for the replies: the same rows, the same silent servo, the same exit code.
    let r = sim.wck(&["--wait", "spin", "--json", "status", "2,0,1"]);
    assert_eq!(r.code, Some(3), "{r:#?}");
    let spun: Value = serde_json::from_str(&r.stdout).unwrap();
    assert_eq!(spun["results"], v["results"]);
    // A wait mode that is none: exit 2, naming the value and the choices.
    let r = sim.wck(&["--wait", "busy", "status", "0"]);
    assert_eq!(r.code, Some(2), "{r:#?}");
    assert!(
        r.stderr.contains("busy") && r.stderr.contains("sleep, spin or spin:"),
        "{}",
        r.stderr
    );
    // Confirmed reads: on request for any read, never both ways at once.
    assert_eq!(
        sim.result(&["--verify-reads", "status", "0"])["position"],
        127
    );
    assert_eq!(
        sim.result(&["--no-verify-reads", "get", "gains", "0"])["id"],
        0
    );
    let r = sim.wck(&["--verify-reads", "--no-verify-reads", "status", "0"]);
    assert_eq!(r.code, Some(2), "{r:#?}");
    // A wrong baud rate: nobody answers.
    let r = sim.wck(&["--baud", "57600", "get", "gains", "0"]);
    assert_eq!(r.code, Some(3), "{r:#?}");
    assert!(r.stderr.contains("57600"), "{}", r.stderr);
    // A port that does not exist: exit 3, naming the path.
    let missing = Path::new(sim.port()).with_file_name("nothing-here");
    let r = robobus(&["wck", "--port", missing.to_str().unwrap(), "status", "0"]);
    assert_eq!(r.code, Some(3), "{r:#?}");
    assert!(r.stderr.contains("nothing-here"), "{}", r.stderr);
}

#[test]
fn scan_finds_servos_flags_duplicates_and_fails_on_an_empty_bus() {
    let sim = Sim::start("0,2,3", &[]);
    let out = sim.ok(&["scan", "--ids", "0-5"]);
    let ids: Vec<&str> = out
        .lines()
        .skip(1)
        .filter(|l| !l.starts_with('#'))
        .map(|l| l.split_whitespace().next().unwrap())
        .collect();
    assert_eq!(ids, ["0", "2", "3"], "{out}");
    assert!(out.contains("3 servo(s) found, 0 duplicate"), "{out}");

    // Every rate: the servos are found at theirs.
    let v = sim.json(&["scan", "--all-bauds", "--ids", "0-2"]);
    assert_eq!(v["op"], "wck.scan");
    assert_eq!(
        v["summary"]["bauds_tried"].as_array().unwrap().len(),
        8,
        "{v}"
    );
    let found = v["results"].as_array().unwrap();
    assert_eq!(found.len(), 2, "{v}");
    assert!(found.iter().all(|f| f["baud"] == 115_200), "{v}");
    assert_eq!(found[0]["id"], 0);
    assert_eq!(found[0]["position"], 127);
    assert_eq!(v["summary"]["duplicates"].as_array().unwrap().len(), 0);

    // Nobody at these IDs: the empty result, then exit 3.
    let r = sim.wck(&["--json", "scan", "--ids", "5-7"]);
    assert_eq!(r.code, Some(3), "{r:#?}");
    let v: Value = serde_json::from_str(&r.stdout).unwrap();
    assert_eq!(v["results"].as_array().unwrap().len(), 0);
    assert_eq!(v["failed"], "no-device");
    assert!(
        r.stderr.contains("5-7") && r.stderr.contains(sim.port()),
        "{}",
        r.stderr
    );

    // Bad input.
    let r = sim.wck(&["scan", "--ids", "0-31"]);
    assert_eq!(r.code, Some(2), "{r:#?}");
}

#[test]
fn scan_flags_two_servos_sharing_an_id() {
    // At 921600 bit/s the replies of two modules with one ID collide visibly.
    let sim = Sim::start("0,1,1", &["--baud", "921600"]);
    // The table names the duplicate, and the exit code is 1 (a device fault), as for
    // `whj scan`.
    let r = sim.wck(&["--baud", "921600", "scan", "--ids", "0-2"]);
    assert_eq!(r.code, Some(1), "{r:#?}");
    assert!(r.stdout.contains("DUPLICATE  ID 1"), "{r:#?}");
    assert!(
        r.stderr.contains("more than one module answers at ID 1"),
        "{r:#?}"
    );
    let r = sim.wck(&["--json", "--baud", "921600", "scan", "--ids", "0-2"]);
    assert_eq!(r.code, Some(1), "{r:#?}");
    let v: Value = serde_json::from_str(&r.stdout).unwrap();
    assert_eq!(v["failed"], "device");
    let dups = v["summary"]["duplicates"].as_array().unwrap();
    assert_eq!(dups.len(), 1, "{v}");
    assert_eq!(dups[0]["id"], 1);
    assert!(!dups[0]["evidence"].as_str().unwrap().is_empty());
    let found: Vec<&Value> = v["results"].as_array().unwrap().iter().collect();
    assert_eq!(found.len(), 1, "{v}");
    assert_eq!(found[0]["id"], 0);
}

#[test]
fn every_parameter_reads_back_what_was_set() {
    let sim = Sim::start("0-1", &[]);
    // EEPROM settings need --yes without a terminal; nothing is sent otherwise.
    let r = sim.wck(&["set", "overload", "1", "1000"]);
    assert_eq!(r.code, Some(2), "{r:#?}");
    assert!(r.stderr.contains("--yes"), "{}", r.stderr);
    let before = sim.result(&["get", "overload", "1"]);
    assert_ne!(before["milliamps"], 1000, "{before}");

    let set = sim.result(&["--yes", "set", "overload", "1", "1000"]);
    assert_eq!(set["milliamps"], 1000, "{set}");
    let got = sim.result(&["get", "overload", "1"]);
    assert_eq!(got["milliamps"], 1000, "{got}");
    assert!(got["overload_code"].is_u64());
    assert_ne!(
        sim.result(&["get", "overload", "0"])["milliamps"],
        1000,
        "servo 0 keeps its own"
    );

    sim.ok(&["--yes", "set", "gains", "1", "30", "20"]);
    let gains = sim.result(&["get", "gains", "1"]);
    assert_eq!(
        (gains["p_gain"].as_u64(), gains["d_gain"].as_u64()),
        (Some(30), Some(20))
    );

    // Runtime gains: no confirmation needed, effective at once.
    let gains = sim.result(&["set", "gains", "1", "40", "25", "--runtime"]);
    assert_eq!(
        (gains["p_gain"].as_u64(), gains["d_gain"].as_u64()),
        (Some(40), Some(25))
    );

    sim.ok(&["--yes", "set", "i-gain", "1", "5"]);
    assert_eq!(sim.result(&["get", "i-gain", "1"])["i_gain"], 5);
    let runtime_i = sim.result(&["set", "i-gain", "1", "3", "--runtime"]);
    assert_eq!(runtime_i["i_gain"], 3);

    sim.ok(&["--yes", "set", "speed", "1", "10", "50"]);
    let speed = sim.result(&["get", "speed", "1"]);
    assert_eq!(
        (speed["speed"].as_u64(), speed["accel"].as_u64()),
        (Some(10), Some(50))
    );
    // The runtime speed set has no reply: the row says so.
    let speed = sim.result(&["set", "speed", "1", "12", "40", "--runtime"]);
    assert!(
        speed["reply"].as_str().unwrap().contains("no reply"),
        "{speed}"
    );
    let speed = sim.result(&["get", "speed", "1"]);
    assert_eq!(
        (speed["speed"].as_u64(), speed["accel"].as_u64()),
        (Some(12), Some(40))
    );

    sim.ok(&["--yes", "set", "bounds", "1", "10", "240"]);
    let bounds = sim.result(&["get", "bounds", "1"]);
    assert_eq!(
        (bounds["lower"].as_u64(), bounds["upper"].as_u64()),
        (Some(10), Some(240))
    );
    assert!(bounds["lower_degrees"].as_f64().unwrap() > 10.0);

    let written = sim.result(&["set", "io", "1", "2"]);
    assert_eq!(written["outputs"], 2);
    let io = sim.result(&["get", "io", "1"]);
    assert_eq!(io["outputs"], 2);
    assert_eq!(io["do1"], false);
    assert_eq!(io["do2"], true);
    assert!(io["adc"].is_u64() && io["adc_volts"].is_f64(), "{io}");

    // Text tables name their columns like the JSON fields.
    let out = sim.ok(&["get", "overload", "1"]);
    assert!(out.starts_with("ID") && out.contains("MILLIAMPS"), "{out}");
    assert!(out.lines().nth(1).unwrap().contains("1000"), "{out}");

    // Bad values: exit 2, named.
    let r = sim.wck(&["--yes", "set", "overload", "1", "2000"]);
    assert_eq!(r.code, Some(2), "{r:#?}");
    assert!(r.stderr.contains("2000"), "{}", r.stderr);
    let r = sim.wck(&["--yes", "set", "bounds", "1", "200", "100"]);
    assert_eq!(r.code, Some(2), "{r:#?}");
    assert_eq!(sim.result(&["get", "bounds", "1"])["lower"], 10);
}

#[test]
fn set_id_and_set_baud_are_verified_and_take_effect() {
    let sim = Sim::start("0-1", &[]);
    let r = sim.result(&["--yes", "set-id", "1", "7"]);
    assert_eq!((r["id"].as_u64(), r["new_id"].as_u64()), (Some(1), Some(7)));
    assert_eq!(sim.position(7), 127);
    let r = sim.wck(&["status", "1"]);
    assert_eq!(r.code, Some(3), "the old ID no longer answers: {r:#?}");
    // An ID that is taken is refused (the client checks first): a refusal, exit code 2
    // (the library's error kind `refused`; nothing changed on the servo).
    let r = sim.wck(&["--yes", "set-id", "7", "0"]);
    assert_eq!(r.code, Some(2), "{r:#?}");
    assert!(r.stderr.contains("already answers"), "{}", r.stderr);
    sim.ok(&["--yes", "set-id", "7", "1"]);
    assert_eq!(sim.position(1), 127);

    let r = sim.result(&["--yes", "set-baud", "1", "57600"]);
    assert_eq!(r["baud"], 57_600);
    assert_eq!(
        sim.result(&["--baud", "57600", "status", "1"])["position"],
        127
    );
    assert_eq!(sim.wck(&["status", "1"]).code, Some(3));
    sim.ok(&["--baud", "57600", "--yes", "set-baud", "1", "115200"]);
    assert_eq!(sim.position(1), 127);
    // Without --yes: refused before anything is sent.
    assert_eq!(sim.wck(&["set-id", "1", "4"]).code, Some(2));
    assert_eq!(sim.position(1), 127);
}

#[test]
fn programs_upload_verified_download_the_count_and_check_offline() {
    let sim = Sim::start("0", &[]);
    let dir = tempfile::tempdir().unwrap();
    let prog = write(
        dir.path(),
        "p.txt",
        "move 100 torque 2\ndelay 300ms\nmove 150 torque 2\nrepeat forever\n",
    );
    let empty = write(dir.path(), "empty.txt", "# nothing\n");
    let bad = write(dir.path(), "bad.txt", "move 300 torque 2\n");
    let p = prog.to_str().unwrap();
    // Check needs no device.
    let out = common::ok(&["wck", "program", "check", p]);
    assert!(out.contains("OK, 4 instruction(s)"), "{out}");

    assert_eq!(sim.result(&["program", "download", "0"])["instructions"], 0);
    let r = sim.result(&["--yes", "program", "upload", "0", p]);
    assert_eq!(r["instructions"], 4);
    assert_eq!(sim.result(&["program", "download", "0"])["instructions"], 4);
    // The program runs: the shaft leaves 127.
    let deadline = Instant::now() + Duration::from_secs(3);
    while sim.position(0).abs_diff(127) <= 2 {
        assert!(
            Instant::now() < deadline,
            "the program does not move the servo"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    // An empty program switches it off.
    sim.ok(&["--yes", "program", "upload", "0", empty.to_str().unwrap()]);
    assert_eq!(sim.result(&["program", "download", "0"])["instructions"], 0);
    // A bad file: exit 2 with file:line:column, nothing sent.
    let r = sim.wck(&["--yes", "program", "upload", "0", bad.to_str().unwrap()]);
    assert_eq!(r.code, Some(2), "{r:#?}");
    assert!(r.stderr.contains("bad.txt:1:"), "{}", r.stderr);
    assert_eq!(sim.result(&["program", "download", "0"])["instructions"], 0);
}

#[test]
fn passive_wheel_brake_and_sync_move() {
    let sim = Sim::start("0-2", &[]);
    let v = sim.json(&["passive", "0-2"]);
    let rows = v["results"].as_array().unwrap();
    assert_eq!(rows.len(), 3);
    assert!(rows.iter().all(|r| r["position"] == 127), "{v}");

    // A synchronized move drives servos 0..N-1 at once (no reply).
    let r = sim.result(&["sync-move", "100", "110", "120"]);
    assert_eq!(r["id"], "all");
    assert_eq!(r["positions"], serde_json::json!([100, 110, 120]));
    sim.wait_at(0, 100);
    sim.wait_at(1, 110);
    sim.wait_at(2, 120);

    // A timed wheel run turns the shaft, then holds it.
    let r = sim.result(&["wheel", "1", "ccw", "10", "--duration", "0.3"]);
    assert_eq!(r["stopped"], "hold");
    assert!(r["ran_ms"].as_u64().unwrap() >= 300, "{r}");
    // It comes to rest (the hold target is the position read as the wheel stopped; a
    // stalled machine lets the shaft run on a little before the hold lands) and stays.
    let stopped = sim.at_rest(1);
    assert_ne!(stopped, 110, "the wheel turned");
    std::thread::sleep(Duration::from_millis(200));
    assert!(sim.position(1).abs_diff(stopped) <= 2, "it holds still");
    // Without a duration the command returns and the servo keeps turning.
    sim.ok(&["wheel", "2", "cw", "15"]);
    let a = sim.position(2);
    std::thread::sleep(Duration::from_millis(200));
    assert_ne!(sim.position(2), a, "still turning");
    sim.ok(&["move", "2", "127"]);

    // Break: every servo answers at once; the command is heard.
    let out = sim.ok(&["brake"]);
    assert!(out.starts_with("ID"), "{out}");
    // On a shared bus the reply proves only that the break was heard: the output says so
    // instead of presenting it as one servo's position.
    assert!(out.contains("read each servo's status"), "{out}");
    let r = sim.result(&["brake"]);
    assert!(
        r["meaning"]
            .as_str()
            .unwrap()
            .contains("the break was heard"),
        "{r}"
    );
    let r = sim.wck(&["wheel", "1", "up", "3"]);
    assert_eq!(r.code, Some(2), "{r:#?}");
    let r = sim.wck(&["wheel", "1", "ccw", "16"]);
    assert_eq!(r.code, Some(2), "{r:#?}");
    let r = sim.wck(&["sync-move"]);
    assert_eq!(r.code, Some(2), "{r:#?}");
}

#[test]
fn play_ends_at_the_last_pose() {
    let sim = Sim::start("0-1", &[]);
    let dir = tempfile::tempdir().unwrap();
    let f = write(
        dir.path(),
        "m.txt",
        "torque 0\npose 200 100 150\npose 300 160 90\nhold 100\npose 200 140 110\n",
    );
    let start = Instant::now();
    let v = sim.json(&["play", f.to_str().unwrap(), "--rate-hz", "25"])["summary"].clone();
    let took = start.elapsed();
    assert_eq!(v["last_positions"], serde_json::json!([140, 110]));
    assert_eq!(v["planned_ms"], 800);
    // One status read every 200 ms watches the servos: at 200, 400, 600 and 800 ms.
    assert_eq!(v["watch_reads"], 4, "{v}");
    assert_eq!(
        v["sent"].as_u64().unwrap(),
        v["moves"].as_u64().unwrap() + 4,
        "{v}"
    );
    assert!(v["duration_ms"].as_u64().unwrap() >= 800, "{v}");
    assert!(took >= Duration::from_millis(800), "{took:?}");
    sim.wait_at(0, 140);
    sim.wait_at(1, 110);
    // Text form.
    let out = sim.ok(&["play", f.to_str().unwrap()]);
    assert!(out.contains("last pose: 140 110"), "{out}");
    // A bad file: exit 2 with file:line:column.
    let bad = write(dir.path(), "bad.txt", "pose 100 1 2\npose 100 1 300\n");
    let r = sim.wck(&["play", bad.to_str().unwrap()]);
    assert_eq!(r.code, Some(2), "{r:#?}");
    assert!(r.stderr.contains("bad.txt:2:"), "{}", r.stderr);
}

#[test]
fn ctrl_c_during_play_holds_the_servos_and_exits_130() {
    let sim = Sim::start("0-1", &[]);
    let dir = tempfile::tempdir().unwrap();
    let f = write(dir.path(), "long.txt", "pose 0 60 60\npose 4000 220 220\n");
    let child = Command::new(env!("CARGO_BIN_EXE_robobus"))
        .args([
            "wck",
            "--port",
            sim.port(),
            "--reply-margin",
            MARGIN,
            "play",
        ])
        .arg(&f)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    std::thread::sleep(Duration::from_millis(1200));
    let out = interrupt(child);
    assert_eq!(out.status.code(), Some(130), "{out:?}");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("interrupted"), "{stderr}");
    assert!(stderr.contains("hold"), "{stderr}");
    // Held where it was stopped: well short of the end, and it stays there.
    let p = sim.position(0);
    assert!(p < 200, "stopped at {p}");
    std::thread::sleep(Duration::from_millis(300));
    assert!(sim.position(0).abs_diff(p) <= 2, "it holds");
}

#[test]
fn teach_at_a_rate_writes_a_file_that_play_accepts() {
    let sim = Sim::start("0-2", &[]);
    let dir = tempfile::tempdir().unwrap();
    let f = dir.path().join("taught.txt");
    let out = sim.ok(&[
        "teach",
        "0-2",
        "--rate-hz",
        "20",
        "--duration",
        "0.4",
        "-o",
        f.to_str().unwrap(),
    ]);
    assert!(out.contains("pose(s) of servo(s) 0-2"), "{out}");
    let text = std::fs::read_to_string(&f).unwrap();
    let poses: Vec<&str> = text.lines().filter(|l| l.starts_with("pose ")).collect();
    assert!(
        (4..=10).contains(&poses.len()),
        "about 0.4 s x 20 Hz poses: {text}"
    );
    assert!(poses.iter().all(|l| l == &"pose 50 127 127 127"), "{text}");
    // The servos were left passive (the default --on-stop).
    assert_eq!(sim.result(&["status", "0"])["load"], 0);
    // The file plays: synchronized moves of servos 0-2 to 127.
    let dry = common::ok(&["wck", "--dry-run", "play", f.to_str().unwrap()]);
    let packets = common::lines(&dry);
    assert!(!packets.is_empty());
    // (and the status reads that watch servos 0, 1, 2 in turn)
    assert!(
        packets.iter().all(|l| l.starts_with("FF 1F 03 7F 7F 7F ")
            || ["FF A0 00 20", "FF A1 00 21", "FF A2 00 22"].contains(l)),
        "{dry}"
    );
    // Playing it back works on the device too.
    sim.ok(&["play", f.to_str().unwrap()]);

    // Poses per keypress (from stdin), JSON on stdout without --output.
    let mut child = Command::new(env!("CARGO_BIN_EXE_robobus"))
        .args(["wck", "--port", sim.port(), "--reply-margin", MARGIN])
        .args(["--json", "teach", "0-1"])
        .args(["--pose-ms", "400"])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    {
        use std::io::Write as _;
        let mut stdin = child.stdin.take().unwrap();
        stdin.write_all(b"\n\nq\n").unwrap();
    }
    let out = child.wait_with_output().unwrap();
    assert!(out.status.success(), "{out:?}");
    let v: Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["op"], "wck.teach");
    let v = &v["summary"];
    assert_eq!(v["ids"], serde_json::json!([0, 1]));
    assert_eq!(v["recorded"], 3);
    let poses = v["poses"].as_array().unwrap();
    assert_eq!(poses.len(), 3, "the first pose and one per Enter: {v}");
    assert!(poses.iter().all(|p| p["ms"] == 400));

    // Teach records servos 0..N-1: other lists are refused before anything is opened.
    let r = sim.wck(&["teach", "1-2", "--duration", "0.2"]);
    assert_eq!(r.code, Some(2), "{r:#?}");
    assert!(r.stderr.contains("0..N-1"), "{}", r.stderr);
    let r = sim.wck(&["teach", "0-1", "--rate-hz", "500"]);
    assert_eq!(r.code, Some(2), "{r:#?}");
}

#[test]
fn ctrl_c_ends_teach_keeps_the_recording_and_exits_130() {
    let sim = Sim::start("0-1", &[]);
    let dir = tempfile::tempdir().unwrap();
    let f = dir.path().join("taught.txt");
    // At a rate without --duration: until Enter or Ctrl-C; stdin stays open (a pipe).
    let mut child = Command::new(env!("CARGO_BIN_EXE_robobus"))
        .args([
            "wck",
            "--port",
            sim.port(),
            "--reply-margin",
            MARGIN,
            "teach",
            "0-1",
            "--rate-hz",
            "20",
        ])
        .args(["--on-stop", "hold", "-o"])
        .arg(&f)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // Stdin stays open (wait_with_output would close it: an end of input ends teach).
    let stdin = child.stdin.take();
    std::thread::sleep(Duration::from_millis(500));
    let out = interrupt(child);
    drop(stdin);
    assert_eq!(out.status.code(), Some(130), "{out:?}");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("hold"), "{stderr}");
    let text = std::fs::read_to_string(&f).unwrap();
    let poses = text.lines().filter(|l| l.starts_with("pose ")).count();
    assert!(poses >= 2, "the poses so far are written: {text}");
    // --on-stop hold: a position move to where each servo stood (nobody moved them).
    assert_eq!(sim.position(0), 127);
    assert_eq!(sim.position(1), 127);

    // Without -o the poses go to stdout as they are recorded: Ctrl-C keeps them too.
    let mut child = Command::new(env!("CARGO_BIN_EXE_robobus"))
        .args(["wck", "--port", sim.port(), "--reply-margin", MARGIN])
        .args(["teach", "0-1", "--rate-hz", "20"])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // Stdin stays open (wait_with_output would close it: an end of input ends teach).
    let stdin = child.stdin.take();
    std::thread::sleep(Duration::from_millis(500));
    let out = interrupt(child);
    drop(stdin);
    assert_eq!(out.status.code(), Some(130), "{out:?}");
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.starts_with("# robobus keyframe motion\n"), "{text}");
    let poses = text.lines().filter(|l| l.starts_with("pose 50 ")).count();
    assert!(poses >= 2, "the poses so far are on stdout: {text}");
}

#[test]
fn doctor_probes_the_servos_and_flags_a_shared_id() {
    // At 921600 bit/s the replies of two modules with one ID collide visibly (at lower
    // rates two identical modules at one angle answer identically).
    let sim = Sim::start("0,2,2", &["--baud", "921600"]);
    let r = robobus(&[
        "doctor",
        "--json",
        "--wck-port",
        sim.port(),
        "--wck-baud",
        "921600",
        "--reply-margin",
        MARGIN,
    ]);
    // A failed check: exit 5.
    assert_eq!(r.code, Some(5), "{r:#?}");
    let v: Value = serde_json::from_str(&r.stdout).unwrap();
    let findings = v["findings"].as_array().unwrap();
    let of = |check: &str| {
        findings
            .iter()
            .find(|f| f["subject"] == sim.port() && f["check"] == check)
            .unwrap_or_else(|| panic!("no {check} finding: {v:#}"))
            .clone()
    };
    let servos = of("servos");
    assert_eq!(servos["status"], "ok", "{v:#}");
    assert!(
        servos["detail"].as_str().unwrap().contains("IDs 0"),
        "{v:#}"
    );
    let dup = of("duplicate-id");
    assert_eq!(dup["status"], "fail", "{v:#}");
    assert!(dup["detail"].as_str().unwrap().contains("ID 2"), "{v:#}");
    assert!(dup["fix"].as_str().unwrap().contains("set-id 2"), "{v:#}");
}

#[test]
fn monitor_records_the_servo_positions_in_degrees() {
    let sim = Sim::start("0-1", &[]);
    sim.ok(&["move", "1", "200"]);
    std::thread::sleep(Duration::from_millis(800));
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("wck.csv");
    let r = robobus(&[
        "monitor",
        "--port",
        sim.port(),
        "--servos",
        "0-1",
        "--rate-hz",
        "10",
        "--duration",
        "1",
        "--record",
        csv.to_str().unwrap(),
        "--reply-margin",
        MARGIN,
    ]);
    assert_eq!(r.code, Some(0), "{r:#?}");
    let text = std::fs::read_to_string(&csv).unwrap();
    let mut lines = text.lines().filter(|l| !l.starts_with('#'));
    assert_eq!(
        lines.next().unwrap(),
        "t_s,s0_deg,s0_deg_per_s,s0_load,s1_deg,s1_deg_per_s,s1_load"
    );
    let last: Vec<f64> = lines
        .next_back()
        .unwrap()
        .split(',')
        .map(|v| v.parse().unwrap_or(f64::NAN))
        .collect();
    // The degrees `wck status` prints: 127 -> 134.0°, 200 -> 211.0° (269° over 255 steps).
    assert!((last[1] - 133.97).abs() < 1.1, "{text}");
    assert!((last[4] - 210.98).abs() < 1.1, "{text}");
}

/// The monitor is a subscriber of the library's telemetry stream: JSON lines number the
/// samples from 0 in order, say none was lost, and give a servo's speed from its second
/// reading on (a standing servo: 0).
#[test]
fn monitor_json_lines_come_from_the_telemetry_stream() {
    let sim = Sim::start("0-1", &[]);
    let r = robobus(&[
        "--json",
        "monitor",
        "--port",
        sim.port(),
        "--servos",
        "0-1",
        "--rate-hz",
        "10",
        "--duration",
        "1",
        "--reply-margin",
        MARGIN,
    ]);
    assert_eq!(r.code, Some(0), "{r:#?}");
    let samples = common::json_lines(&r.stdout);
    assert!(samples.len() >= 3, "{}", r.stdout);
    let mut t = -1.0;
    for (n, s) in samples.iter().enumerate() {
        assert_eq!(s["sample"], n as u64 + 1, "{s}");
        assert_eq!(s["lost"], 0, "{s}");
        assert!(s["late"].is_boolean(), "{s}");
        let ts = s["t_s"].as_f64().unwrap();
        assert!(ts > t, "{s}");
        t = ts;
        for c in s["channels"].as_array().unwrap() {
            assert_eq!(c["stale"], false, "{s}");
            if n == 0 {
                assert!(c["speed_deg_per_s"].is_null(), "{s}");
            } else {
                assert_eq!(c["speed_deg_per_s"].as_f64(), Some(0.0), "{s}");
            }
        }
    }
}

#[test]
fn ctrl_c_during_a_timed_wheel_run_holds_the_servo_and_exits_130() {
    let sim = Sim::start("0-1", &[]);
    let child = Command::new(env!("CARGO_BIN_EXE_robobus"))
        .args(["wck", "--port", sim.port(), "--reply-margin", MARGIN])
        .args(["--json", "wheel", "1", "ccw", "10", "--duration", "20"])
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // The run holds the port (a second client is refused as busy, without a repeated
    // message); let the wheel turn a while.
    std::thread::sleep(Duration::from_millis(700));
    let busy = sim.wck(&["status", "1"]);
    assert_eq!(busy.code, Some(1), "{busy:#?}");
    assert_eq!(busy.stderr.matches("is busy").count(), 1, "{}", busy.stderr);
    let started = Instant::now();
    let out = interrupt(child);
    assert_eq!(out.status.code(), Some(130), "{out:#?}");
    assert!(
        started.elapsed() < Duration::from_secs(10),
        "Ctrl-C ended the 20 s run"
    );
    // Held (the default --on-stop): it comes to rest and stays.
    let stopped = sim.at_rest(1);
    assert!(stopped.abs_diff(127) > 3, "the wheel turned (at {stopped})");
    std::thread::sleep(Duration::from_millis(300));
    assert!(sim.position(1).abs_diff(stopped) <= 2, "it holds still");
}

#[test]
fn monitor_reads_a_robot_file_as_joint_angles() {
    let sim = Sim::start("0-1", &[]);
    sim.ok(&["move", "1", "200"]);
    sim.wait_at(1, 200);
    let dir = tempfile::tempdir().unwrap();
    let robot = write(
        dir.path(),
        "robot.toml",
        &format!(
            r#"
[buses.legs]
kind = "wck"
port = "{}"

[[joints]]
name = "left knee"
bus = "legs"
id = 1
direction = -1
offset = 0.05
limits = [-1.5, 0.2]
max_velocity = 1.0
max_acceleration = 1.0

[[joints]]
name = "hip"
bus = "legs"
id = 0
limits = [-1.0, 1.0]
max_velocity = 1.0
max_acceleration = 1.0
"#,
            sim.port()
        ),
    );
    let csv = dir.path().join("robot.csv");
    let r = robobus(&[
        "--json",
        "monitor",
        "--robot",
        robot.to_str().unwrap(),
        "--rate-hz",
        "10",
        "--duration",
        "1",
        "--reply-margin",
        MARGIN,
        "--record",
        csv.to_str().unwrap(),
    ]);
    assert_eq!(r.code, Some(0), "{r:#?}");
    let samples = common::json_lines(&r.stdout);
    assert!(samples.len() >= 3, "{}", r.stdout);
    let last = &samples.last().unwrap()["channels"];
    // Step 200 is 73 steps of 269/255° past the centre (127); the knee is mirrored
    // about 0.05 rad.
    let knee = -(73.0 * 269.0 / 255.0 - 0.05f64.to_degrees());
    let got = last[0]["position_deg"].as_f64().unwrap();
    assert_eq!(last[0]["name"], "left knee");
    assert!((got - knee).abs() < 1.1, "{got} vs {knee}: {last}");
    assert!(
        last[1]["position_deg"].as_f64().unwrap().abs() < 1.1,
        "{last}"
    );
    assert!(last[1]["load"].is_number(), "{last}");
    // The recording names the joints.
    let text = std::fs::read_to_string(&csv).unwrap();
    assert!(
        text.lines().any(|l| l
            == "t_s,left_knee_deg,left_knee_deg_per_s,left_knee_load,hip_deg,hip_deg_per_s,hip_load"),
        "{text}"
    );
}

#[test]
fn monitor_refuses_robot_files_it_cannot_open() {
    let dir = tempfile::tempdir().unwrap();
    // A robot file the monitor cannot open: bad input, named.
    let ext = write(
        dir.path(),
        "ext.toml",
        "[buses.legs]\nkind = \"wck-external\"\n[[joints]]\nname = \"a\"\nbus = \"legs\"\n\
         id = 0\nlimits = [-1.0, 1.0]\nmax_velocity = 1.0\nmax_acceleration = 1.0\n",
    );
    let r = robobus(&[
        "monitor",
        "--robot",
        ext.to_str().unwrap(),
        "--duration",
        "1",
    ]);
    assert_eq!(r.code, Some(2), "{r:#?}");
    assert!(
        r.stderr.contains("wck-external") && r.stderr.contains("legs"),
        "{}",
        r.stderr
    );
    // A port that is not there: no device (3).
    let gone = write(
        dir.path(),
        "gone.toml",
        &std::fs::read_to_string(&ext).unwrap().replace(
            "wck-external\"",
            "wck\"\nport = \"/dev/robobus-no-such-port\"",
        ),
    );
    let r = robobus(&[
        "monitor",
        "--robot",
        gone.to_str().unwrap(),
        "--duration",
        "1",
    ]);
    assert_eq!(r.code, Some(3), "{r:#?}");
    assert!(
        r.stderr.contains("/dev/robobus-no-such-port"),
        "{}",
        r.stderr
    );
}

/// On a terminal, `scan` shows its progress on stderr (indicatif), and the table still
/// goes to stdout.
#[test]
fn scan_shows_a_progress_bar_on_a_terminal() {
    use robobus_link::{ByteLink as _, PtyOptions, PtyPair};

    let sim = Sim::start("0-1", &[]);
    let mut pair = PtyPair::open(&PtyOptions::default()).unwrap();
    let tty = std::fs::OpenOptions::new()
        .read(true)
        .write(true)
        .open(&pair.slave_path)
        .unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_robobus"))
        .args(["wck", "--port", sim.port(), "--reply-margin", MARGIN])
        .args(["scan", "--ids", "0-3"])
        .env("COLUMNS", "100")
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(tty)
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(0), "{out:#?}");
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(stdout.starts_with("ID"), "{stdout}");
    let mut drawn = Vec::new();
    let mut buf = [0u8; 4096];
    let until = Instant::now() + Duration::from_millis(500);
    while let Ok(n) = pair.master.read_some(&mut buf, until) {
        if n == 0 {
            break;
        }
        drawn.extend_from_slice(&buf[..n]);
    }
    let drawn = String::from_utf8_lossy(&drawn);
    assert!(drawn.contains("scan"), "{drawn:?}");
    assert!(
        drawn.contains("wck.scan") && drawn.contains("/4"),
        "{drawn:?}"
    );
    // The table is not on the terminal's stderr.
    assert!(!drawn.contains("position"), "{drawn:?}");
}

#[test]
fn teach_reading_keys_from_an_endless_input_ends_it_without_growing() {
    let sim = Sim::start("0-1", &[]);
    let start = Instant::now();
    let out = Command::new(env!("CARGO_BIN_EXE_robobus"))
        .args([
            "--json",
            "wck",
            "--port",
            sim.port(),
            "--reply-margin",
            MARGIN,
            "teach",
            "0-1",
            "--pose-ms",
            "400",
        ])
        .stdin(std::fs::File::open("/dev/zero").unwrap())
        .output()
        .unwrap();
    assert!(out.status.success(), "{out:?}");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("more than 1024 bytes"), "{err}");
    assert!(start.elapsed() < Duration::from_secs(10));
}

#[test]
fn settings_back_up_diff_and_restore_between_servos_and_to_the_factory() {
    let sim = Sim::start("0-1", &[]);
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("s1.json");
    let file_s = file.to_str().unwrap();
    sim.ok(&["--yes", "set", "gains", "1", "30", "20"]);
    sim.ok(&["--yes", "set", "speed", "1", "12", "40"]);
    sim.ok(&["backup", "1", "-o", file_s]);
    let doc: Value = serde_json::from_str(&std::fs::read_to_string(&file).unwrap()).unwrap();
    assert_eq!(doc["format"], "robobus-wck-settings");
    assert_eq!(
        (doc["servo"].as_u64(), doc["p_gain"].as_u64()),
        (Some(1), Some(30))
    );
    // Servo 0 differs in the gains and the speed, from the file and from servo 1.
    for args in [
        &["diff", "0", file_s][..],
        &["diff", "0", "--with", "1"][..],
    ] {
        let rows = sim.json(args)["results"].clone();
        let groups: Vec<&str> = rows
            .as_array()
            .unwrap()
            .iter()
            .map(|r| r["setting"].as_str().unwrap())
            .collect();
        assert_eq!(groups, ["gains", "speed"], "{args:?}");
    }
    // Without --yes nothing is written; with it, only what differs.
    let r = sim.wck(&["restore", "0", file_s]);
    assert_eq!(r.code, Some(2), "{r:#?}");
    assert_eq!(
        sim.json(&["diff", "0", file_s])["results"]
            .as_array()
            .unwrap()
            .len(),
        2
    );
    let restored = sim.json(&["--yes", "restore", "0", file_s]);
    assert_eq!(restored["summary"]["written"], 2, "{restored}");
    assert!(
        sim.json(&["diff", "0", "--with", "1"])["results"]
            .as_array()
            .unwrap()
            .is_empty()
    );
    // The factory settings (A-5).
    sim.ok(&["--yes", "restore", "1", "--factory"]);
    assert!(
        sim.json(&["diff", "1", "--factory"])["results"]
            .as_array()
            .unwrap()
            .is_empty()
    );
    assert_eq!(sim.result(&["get", "gains", "1"])["p_gain"], 20);
    // Bad input is refused before the port is opened.
    let r = common::robobus(&["wck", "--port", "/nonexistent", "diff", "0"]);
    assert_eq!(r.code, Some(2), "{r:#?}");
}

#[test]
fn tune_measures_each_gain_set_and_names_the_best() {
    let sim = Sim::start("0-1", &[]);
    let r = sim.json(&[
        "tune",
        "1",
        "--gains",
        "2,0",
        "--gains",
        "20,30",
        "--hold-ms",
        "600",
    ]);
    let rows = r["results"].as_array().unwrap();
    assert_eq!(rows.len(), 2);
    assert_eq!(r["summary"]["best"], 1, "{r}");
    // The default gains settle sooner than P 2 on the simulated mechanics.
    assert!(
        rows[1]["settling_ms"].as_f64().unwrap() < rows[0]["settling_ms"].as_f64().unwrap(),
        "{r}"
    );
    // Back where it was when the command returned: the first reading after it.
    let start = r["summary"]["start"].as_u64().unwrap();
    assert_eq!(sim.position(1), start);
    // The text names the best set; keeping it in EEPROM needs --yes.
    let text = sim.ok(&["tune", "1", "--gains", "20,30", "--hold-ms", "200"]);
    assert!(text.contains("best: P 20 D 30"), "{text}");
    let r = sim.wck(&["tune", "1", "--gains", "20,30", "--keep", "eeprom"]);
    assert_eq!(r.code, Some(2), "{r:#?}");
    let r = sim.wck(&["tune", "1", "--gains", "20,30", "--amplitude", "80"]);
    assert_eq!(r.code, Some(2), "{r:#?}");
    assert!(r.stderr.contains("--amplitude"), "{}", r.stderr);
}
