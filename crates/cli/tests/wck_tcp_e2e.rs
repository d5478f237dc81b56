//! End to end over TCP: `robobus sim wck --listen 127.0.0.1:0` in its own process, and
//! `robobus wck --port socket://...` against it (the way a user without ptys runs them):
//! the announced address, scan / status / move, the packets a run writes equal to its
//! dry run, one client at a time and the next once it leaves, a port nobody listens on,
//! and bad input.
#![allow(clippy::unwrap_used, clippy::panic)] // test helpers: a failed unwrap is a failed test

use crate::common;

use std::io::{BufRead as _, BufReader};
use std::net::{TcpListener, TcpStream};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use common::{Run, robobus};
use robobus_link::capture::Dir;
use serde_json::Value;

/// `--reply-margin` for the clients, in ms: the simulator is another process on the wall
/// clock (see `wck_e2e.rs`).
const MARGIN: &str = "300";

/// `robobus sim wck --listen 127.0.0.1:0` in its own process; killed on drop.
struct TcpSim {
    child: Child,
    port: String,
}

impl TcpSim {
    fn start(servos: &str) -> Self {
        Self::start_with(servos, &[])
    }

    fn start_with(servos: &str, extra: &[&str]) -> Self {
        let mut child = Command::new(env!("CARGO_BIN_EXE_robobus"))
            .args(["sim", "wck", "--servos", servos, "--listen", "127.0.0.1:0"])
            .args(extra)
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .unwrap();
        let mut first = String::new();
        BufReader::new(child.stdout.take().unwrap())
            .read_line(&mut first)
            .unwrap();
        let port = first.trim().to_owned();
        Self { child, port }
    }

    fn wck(&self, args: &[&str]) -> Run {
        let mut all = vec!["wck", "--port", &self.port, "--reply-margin", MARGIN];
        all.extend_from_slice(args);
        robobus(&all)
    }

    #[track_caller]
    fn json(&self, args: &[&str]) -> Value {
        let mut all = vec!["--json"];
        all.extend_from_slice(args);
        let r = self.wck(&all);
        assert_eq!(r.code, Some(0), "wck {args:?}: {r:#?}");
        serde_json::from_str(&r.stdout).unwrap()
    }

    #[track_caller]
    fn position(&self, id: u8) -> u64 {
        self.json(&["status", &id.to_string()])["results"][0]["position"]
            .as_u64()
            .unwrap()
    }
}

impl Drop for TcpSim {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

#[test]
fn the_simulator_announces_the_port_it_chose_and_scan_status_move_work_over_it() {
    let sim = TcpSim::start("0-5");
    let addr = sim
        .port
        .strip_prefix("socket://127.0.0.1:")
        .unwrap_or_else(|| panic!("announced {:?}", sim.port));
    assert_ne!(addr.parse::<u16>().unwrap(), 0, "{}", sim.port);

    let scan = sim.json(&["scan"]);
    let found: Vec<u64> = scan["results"]
        .as_array()
        .unwrap()
        .iter()
        .map(|r| r["id"].as_u64().unwrap())
        .collect();
    assert_eq!(found, [0, 1, 2, 3, 4, 5], "{scan}");

    assert_eq!(sim.position(3), 127);
    let moved = sim.json(&["move", "2", "100"]);
    assert_eq!(moved["results"][0]["position_before"], 127, "{moved}");
    assert_eq!(moved["bus"], sim.port.as_str(), "{moved}");
    let deadline = Instant::now() + Duration::from_secs(3);
    while sim.position(2).abs_diff(100) > 3 {
        assert!(Instant::now() < deadline, "servo 2 never reached 100");
        std::thread::sleep(Duration::from_millis(50));
    }
    // The others stayed where they were.
    assert_eq!(sim.position(3), 127);
}

/// The packets of a run over TCP, from its capture, are those its dry run prints.
#[test]
fn a_run_over_tcp_writes_exactly_the_packets_of_its_dry_run() {
    let sim = TcpSim::start("0-3");
    let dir = tempfile::tempdir().unwrap();
    for (i, args) in [
        &["move", "2", "100"][..],
        &["status", "3"],
        &["move", "1", "--torque", "2", "50"],
    ]
    .iter()
    .enumerate()
    {
        let capture = dir.path().join(format!("run{i}.hex"));
        let mut all = vec!["--capture", capture.to_str().unwrap()];
        all.extend_from_slice(args);
        let r = sim.wck(&all);
        assert_eq!(r.code, Some(0), "{args:?}: {r:#?}");
        let written: Vec<String> =
            robobus_link::read_hex_log(BufReader::new(std::fs::File::open(&capture).unwrap()))
                .unwrap()
                .into_iter()
                .filter(|r| r.dir == Dir::Written)
                .map(|r| {
                    r.bytes
                        .iter()
                        .map(|b| format!("{b:02X}"))
                        .collect::<Vec<_>>()
                        .join(" ")
                })
                .collect();
        let mut dry_args = vec!["wck", "--port", &sim.port, "--dry-run"];
        dry_args.extend_from_slice(args);
        let dry = common::ok(&dry_args);
        assert_eq!(written, common::lines(&dry), "{args:?}");
    }
}

/// One client at a time: a connection made while another is held is closed at once
/// (the command fails naming the address), and the next is served once it leaves, as a
/// serial port closed and opened again.
#[test]
fn a_second_client_is_turned_away_while_one_is_connected_and_served_after() {
    let sim = TcpSim::start("0");
    let addr = sim.port.strip_prefix("socket://").unwrap();
    let held = TcpStream::connect(addr).unwrap();
    // The simulator takes the held connection as its client when it next looks.
    std::thread::sleep(Duration::from_millis(100));
    let r = sim.wck(&["status", "0"]);
    assert_eq!(r.code, Some(1), "{r:#?}");
    assert!(
        r.stderr.contains(&sim.port) && r.stderr.contains("one at a time"),
        "{}",
        r.stderr
    );
    drop(held);
    assert_eq!(sim.position(0), 127);
    // And again: every command is a connection closed at its end.
    assert_eq!(sim.position(0), 127);
}

/// A port nobody listens on is a missing device (exit 3), named with a hint.
#[test]
fn a_socket_nobody_listens_on_exits_3_naming_it() {
    let free = TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap();
    let port = format!("socket://{free}");
    let r = robobus(&["wck", "--port", &port, "status", "0"]);
    assert_eq!(r.code, Some(3), "{r:#?}");
    assert!(
        r.stderr.contains(&port)
            && r.stderr.contains("nothing answers")
            && r.stderr.contains("refused"),
        "{}",
        r.stderr
    );
}

/// Bad `--port` and `--listen` values exit 2 naming the value and the forms allowed;
/// nothing is opened (a dry run of the simulator binds nothing, even where a bind fails).
#[test]
fn bad_ports_and_listen_addresses_exit_2_and_nothing_is_opened() {
    for (port, why) in [
        ("socket://127.0.0.1", "no port"),
        ("socket://127.0.0.1:0", "port 0"),
        ("socket://127.0.0.1:99999", "1..=65535"),
        ("rfc2217://127.0.0.1:5600", "only socket://"),
        ("COM0", "COM1..=COM256"),
    ] {
        let r = robobus(&["wck", "--port", port, "status", "0"]);
        assert_eq!(r.code, Some(2), "{port}: {r:#?}");
        assert!(
            r.stderr.contains(port) && r.stderr.contains(why) && r.stderr.contains("COM3"),
            "{port}: {}",
            r.stderr
        );
        let r = robobus(&["monitor", "--port", port, "--servos", "0"]);
        assert_eq!(r.code, Some(2), "monitor {port}: {r:#?}");
    }
    for listen in ["nonsense", "127.0.0.1", "localhost:5600", "127.0.0.1:65536"] {
        let r = robobus(&["sim", "wck", "--listen", listen]);
        assert_eq!(r.code, Some(2), "{listen}: {r:#?}");
        assert!(
            r.stderr.contains(listen) && r.stderr.contains("127.0.0.1:5600"),
            "{listen}: {}",
            r.stderr
        );
    }
    // An address in use: the dry run does not notice (it binds nothing), the run does.
    let taken = TcpListener::bind("127.0.0.1:0").unwrap();
    let addr = taken.local_addr().unwrap().to_string();
    let dry = robobus(&["--dry-run", "sim", "wck", "--listen", &addr]);
    assert_eq!(dry.code, Some(0), "{dry:#?}");
    assert!(
        dry.stdout.contains(&format!("on TCP {addr}")) && dry.stdout.contains("nothing opened"),
        "{}",
        dry.stdout
    );
    let r = robobus(&["sim", "wck", "--listen", &addr]);
    assert_eq!(r.code, Some(2), "{r:#?}");
    assert!(r.stderr.contains(&addr), "{}", r.stderr);
}

/// A Windows COM name outside Windows is "not available here" (exit 4), naming what to
/// use instead.
#[cfg(not(windows))]
#[test]
fn a_com_port_outside_windows_exits_4_naming_the_device_paths() {
    let r = robobus(&["wck", "--port", "COM7", "status", "0"]);
    assert_eq!(r.code, Some(4), "{r:#?}");
    assert!(
        r.stderr.contains("COM7") && r.stderr.contains("/dev/"),
        "{}",
        r.stderr
    );
}

/// The simulator's capture and wire faults work over TCP as on the pty: the capture holds
/// what the servos received and sent.
#[test]
fn the_simulator_captures_its_tcp_traffic() {
    let dir = tempfile::tempdir().unwrap();
    let capture = dir.path().join("sim.hex");
    let sim = TcpSim::start_with("0-1", &["--capture", capture.to_str().unwrap()]);
    assert_eq!(sim.position(1), 127);
    drop(sim);
    let records =
        robobus_link::read_hex_log(BufReader::new(std::fs::File::open(&capture).unwrap())).unwrap();
    // The servos' side: the status read of servo 1 came in, its reply went out.
    let status = [0xFF, 0xA1, 0x00, 0x21];
    let read: Vec<u8> = records
        .iter()
        .filter(|r| r.dir == Dir::Read)
        .flat_map(|r| r.bytes.clone())
        .collect();
    assert!(read.windows(4).any(|w| w == status), "{records:?}");
    let written: Vec<u8> = records
        .iter()
        .filter(|r| r.dir == Dir::Written)
        .flat_map(|r| r.bytes.clone())
        .collect();
    assert!(written.ends_with(&[0x00, 0x7F]), "{records:?}");
}
