//! End to end on Windows: the Windows build of `robobus` (`robobus.exe`, cross-compiled for
//! `x86_64-pc-windows-gnu`) run under wine against simulators running on Linux: the built-in
//! simulated robot (`demo`, `run`), six wCK servos of `robobus sim wck` on a pty that wine
//! maps to `COM7`, and WHJ joints behind the slcan adapter `robobus sim whj --bus slcan:PATH`
//! emulates on a pty that wine maps to `COM8`.
//!
//! A plain `cargo test` has no Windows build, so these tests are `#[ignore]`d there;
//! `scripts/wine/test-windows` builds `robobus.exe` and runs them with
//! `ROBOBUS_WINDOWS_EXE` naming it. Run that way without the variable, they fail.
#![cfg(target_os = "linux")]
#![allow(clippy::unwrap_used, clippy::panic)] // test helpers: a failed unwrap is a failed test

use crate::common;

use std::io::{BufRead as _, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use common::Run;
use serde_json::Value;

/// The longest a run of `robobus.exe` under wine may take (wine's own start included).
const RUN_LIMIT: Duration = Duration::from_secs(120);

/// `--reply-margin` for the wCK clients, in ms: the simulator is another process on the
/// wall clock, and wine adds its own latency to every read of the COM port.
const MARGIN: &str = "300";

/// `robobus.exe` and the wine prefix it runs in.
struct Wine {
    exe: PathBuf,
    prefix: PathBuf,
}

impl Wine {
    /// The exe `ROBOBUS_WINDOWS_EXE` names and the workspace's wine prefix
    /// (`scripts/wine/ensure-wine` makes it, with what a Rust .exe needs under wine 8.0).
    fn new() -> Self {
        let exe = std::env::var_os("ROBOBUS_WINDOWS_EXE").map_or_else(
            || panic!("ROBOBUS_WINDOWS_EXE is not set: run scripts/wine/test-windows, which builds robobus.exe for x86_64-pc-windows-gnu and runs these tests with it"),
            PathBuf::from,
        );
        assert!(
            exe.is_file(),
            "ROBOBUS_WINDOWS_EXE={} is not a file",
            exe.display()
        );
        let prefix = PathBuf::from(robobus_testkit::provision("wine/ensure-wine"));
        Self { exe, prefix }
    }

    /// `robobus.exe ARGS` under wine (scripts/wine/run), at most [`RUN_LIMIT`].
    fn run(&self, args: &[&str]) -> Run {
        let runner = robobus_testkit::workspace_root().join("scripts/wine/run");
        let mut child = Command::new(runner)
            .env("WINEPREFIX", &self.prefix)
            .env("WINEDEBUG", "-all")
            .env_remove("RUST_LOG")
            .env("COLUMNS", "100")
            .arg(&self.exe)
            .args(args)
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        let stdout = drain(child.stdout.take().unwrap());
        let stderr = drain(child.stderr.take().unwrap());
        let start = Instant::now();
        let status = loop {
            if let Some(status) = child.try_wait().unwrap() {
                break status;
            }
            if start.elapsed() > RUN_LIMIT {
                let _ = child.kill();
                let _ = child.wait();
                panic!(
                    "robobus.exe {args:?} still runs after {RUN_LIMIT:?}: killed; stderr: {}",
                    stderr.join().unwrap()
                );
            }
            std::thread::sleep(Duration::from_millis(20));
        };
        Run {
            code: status.code(),
            stdout: stdout.join().unwrap(),
            stderr: stderr.join().unwrap(),
        }
    }

    /// Like [`Wine::run`] and requires exit code 0; returns stdout.
    #[track_caller]
    fn ok(&self, args: &[&str]) -> String {
        let r = self.run(args);
        assert_eq!(r.code, Some(0), "robobus.exe {args:?}: {r:#?}");
        r.stdout
    }

    /// Like [`Wine::ok`] with `--json` after the subcommand's first word; parsed.
    #[track_caller]
    fn json(&self, args: &[&str]) -> Value {
        let out = self.ok(args);
        serde_json::from_str(&out)
            .unwrap_or_else(|e| panic!("robobus.exe {args:?}: not JSON ({e}): {out}"))
    }

    /// Makes `COMn` of the prefix the Linux device `target` (a symlink in `dosdevices`,
    /// which is how wine maps COM ports); removed again on drop.
    fn com_port(&self, n: u8, target: &Path) -> ComPort {
        let link = self.prefix.join("dosdevices").join(format!("com{n}"));
        // Wine's own `comN` (a /dev/ttyS* it found at boot) or one a killed run left.
        let _ = std::fs::remove_file(&link);
        std::os::unix::fs::symlink(target, &link).unwrap();
        ComPort { link }
    }
}

/// Reads `from` to its end on a thread of its own (a child never blocks on a full pipe).
fn drain(mut from: impl std::io::Read + Send + 'static) -> std::thread::JoinHandle<String> {
    std::thread::spawn(move || {
        let mut bytes = Vec::new();
        let _ = from.read_to_end(&mut bytes);
        String::from_utf8_lossy(&bytes).into_owned()
    })
}

/// A COM port of the wine prefix, mapped to a Linux device until dropped.
struct ComPort {
    link: PathBuf,
}

impl Drop for ComPort {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.link);
    }
}

/// A Linux path as a Windows program under wine names it (drive `Z:` is `/`).
fn windows_path(path: &Path) -> String {
    format!("Z:{}", path.to_str().unwrap().replace('/', "\\"))
}

/// A Linux `robobus sim ...` (the Linux build of this crate) in its own process, killed
/// (SIGTERM, then SIGKILL) on drop.
struct LinuxSim {
    child: Child,
}

impl LinuxSim {
    /// `robobus sim ARGS`, up once its standard error has a line containing `ready`.
    fn start(args: &[&str], ready: &str) -> Self {
        let mut child = Command::new(env!("CARGO_BIN_EXE_robobus"))
            .arg("sim")
            .args(args)
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        let out = drain(child.stdout.take().unwrap());
        let mut err = BufReader::new(child.stderr.take().unwrap());
        let start = Instant::now();
        let mut seen = String::new();
        while !seen.contains(ready) {
            let mut line = String::new();
            let n = err.read_line(&mut line).unwrap();
            assert!(
                n > 0,
                "robobus sim {args:?} exited: {seen}{}",
                out.join().unwrap()
            );
            assert!(
                start.elapsed() < Duration::from_secs(20),
                "robobus sim {args:?} did not start: {seen}"
            );
            seen.push_str(&line);
        }
        // Keep draining standard error so the simulator never blocks on a full pipe.
        std::thread::spawn(move || std::io::copy(&mut err, &mut std::io::sink()));
        Self { child }
    }
}

impl Drop for LinuxSim {
    fn drop(&mut self) {
        common::terminate(&mut self.child);
    }
}

fn f(v: &Value) -> f64 {
    v.as_f64().unwrap_or_else(|| panic!("not a number: {v}"))
}

#[test]
#[ignore = "needs the Windows robobus.exe: scripts/wine/test-windows builds it and runs these tests with ROBOBUS_WINDOWS_EXE"]
fn windows_exe_runs_the_demo_on_the_built_in_simulated_robot() {
    let wine = Wine::new();
    let doc = wine.json(&["demo", "--seconds", "1", "--json"]);
    // The whole robot is found and driven (the tracking figures are the wall clock's under
    // wine, not robobus's: the Linux demo test checks them).
    assert_eq!(doc["wck"]["servos_found"], 16, "{doc}");
    assert_eq!(doc["wck"]["poses"].as_array().unwrap().len(), 3, "{doc}");
    let whj = &doc["whj"];
    assert_eq!(whj["joints"], 7, "{whj}");
    assert!(
        whj["identities"]
            .as_array()
            .unwrap()
            .iter()
            .all(|i| i["model"] == "WHJ30"),
        "{whj}"
    );
    assert!(f(&whj["cycles"]) > 0.0, "{whj}");
    for t in whj["tracking"].as_array().unwrap() {
        assert!(f(&t["samples"]) > 0.0, "{t}");
    }
}

#[test]
#[ignore = "needs the Windows robobus.exe: scripts/wine/test-windows builds it and runs these tests with ROBOBUS_WINDOWS_EXE"]
fn windows_exe_runs_a_request_file_as_the_linux_build_does() {
    let wine = Wine::new();
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("requests.json");
    std::fs::write(
        &file,
        r#"[{"op":"wck.status","ids":"0-2"},{"op":"wck.move","id":1,"position":200,"torque":1},
            {"op":"whj.scan","joints":"1-7"},{"op":"whj.info","joint":3}]"#,
    )
    .unwrap();
    // The file by its Windows name, on the built-in simulated robot.
    let windows = wine.ok(&["run", &windows_path(&file)]);
    let linux = common::ok(&["run", file.to_str().unwrap()]);
    let doc: Value = serde_json::from_str(&windows).unwrap();
    assert_eq!(doc.as_array().unwrap().len(), 4, "{doc}");
    assert_eq!(doc[1]["results"][0]["position_before"], 127, "{doc}");
    assert_eq!(doc[2]["results"].as_array().unwrap().len(), 7, "{doc}");
    // Byte for byte what the Linux build reports (line ends aside).
    assert_eq!(windows.replace("\r\n", "\n"), linux);
    // A request that is bad input: exit 2 before anything runs, as on Linux.
    std::fs::write(&file, r#"{"op":"wck.move","id":1,"position":255}"#).unwrap();
    let r = wine.run(&["run", &windows_path(&file)]);
    assert_eq!(r.code, Some(2), "{r:#?}");
    assert!(r.stderr.contains("255"), "{}", r.stderr);
}

#[test]
#[ignore = "needs the Windows robobus.exe: scripts/wine/test-windows builds it and runs these tests with ROBOBUS_WINDOWS_EXE"]
fn windows_exe_scans_reads_and_moves_six_wck_servos_of_a_linux_simulator_through_com7() {
    let wine = Wine::new();
    let dir = tempfile::tempdir().unwrap();
    let pty = dir.path().join("wck");
    let _sim = LinuxSim::start(
        &[
            "wck",
            "--servos",
            "0-5",
            "--eeprom-ms",
            "5",
            "--link",
            pty.to_str().unwrap(),
        ],
        "Ctrl-C stops",
    );
    let _com7 = wine.com_port(7, &pty);
    let wck = |args: &[&'static str]| {
        [&["wck", "--port", "COM7", "--reply-margin", MARGIN], args].concat()
    };

    // Scan (every ID, as a user scans): the six servos, at the factory position, on COM7.
    let scan = wine.json(&wck(&["--json", "scan"]));
    assert_eq!(scan["bus"], "COM7", "{scan}");
    let found: Vec<&Value> = scan["results"].as_array().unwrap().iter().collect();
    assert_eq!(
        found
            .iter()
            .map(|r| r["id"].as_u64().unwrap())
            .collect::<Vec<_>>(),
        [0, 1, 2, 3, 4, 5],
        "{scan}"
    );
    assert!(found.iter().all(|r| r["position"] == 127), "{scan}");
    // Status: a table with one row per servo.
    let table = wine.ok(&wck(&["status", "0-5"]));
    let rows: Vec<Vec<&str>> = table
        .lines()
        .skip(1)
        .map(|l| l.split_whitespace().collect())
        .collect();
    assert_eq!(rows.len(), 6, "{table}");
    for (id, row) in rows.iter().enumerate() {
        assert_eq!(row[0], id.to_string(), "{table}");
        assert_eq!(row[2], "127", "{table}");
    }

    // Move: the reply is the status before it; the servo gets there, the others stay.
    let m = wine.json(&wck(&["--json", "move", "2", "200", "--torque", "1"]));
    assert_eq!(m["results"][0]["target_position"], 200, "{m}");
    assert_eq!(m["results"][0]["position_before"], 127, "{m}");
    let deadline = Instant::now() + Duration::from_secs(20);
    loop {
        let s = wine.json(&wck(&["--json", "status", "2"]));
        let p = s["results"][0]["position"].as_u64().unwrap();
        if p.abs_diff(200) <= 3 {
            break;
        }
        assert!(Instant::now() < deadline, "servo 2 stays at {p}: {s}");
        std::thread::sleep(Duration::from_millis(100));
    }
    let s = wine.json(&wck(&["--json", "status", "0"]));
    assert_eq!(s["results"][0]["position"], 127, "servo 0 moved: {s}");

    // A servo that does not answer: exit 3, as on Linux.
    let r = wine.run(&wck(&["status", "9"]));
    assert_eq!(r.code, Some(3), "{r:#?}");
}

#[test]
#[ignore = "needs the Windows robobus.exe: scripts/wine/test-windows builds it and runs these tests with ROBOBUS_WINDOWS_EXE"]
fn windows_exe_reads_and_moves_whj_joints_behind_an_emulated_slcan_adapter_through_com8() {
    let wine = Wine::new();
    let dir = tempfile::tempdir().unwrap();
    let pty = dir.path().join("slcan");
    let bus = format!("slcan:{}", pty.to_str().unwrap());
    let _sim = LinuxSim::start(
        &["whj", "--joints", "1-7", "--seed", "3", "--bus", &bus],
        "serving",
    );
    let _com8 = wine.com_port(8, &pty);
    let whj = |args: &[&str]| {
        let mut all = vec!["whj", "--bus", "slcan:COM8", "--json"];
        all.extend_from_slice(args);
        wine.json(&all)
    };

    // Status of all seven joints, read through the adapter.
    let st = whj(&["status", "1-7"]);
    assert_eq!(st["bus"], "slcan:COM8", "{st}");
    let rows = st["results"].as_array().unwrap();
    assert_eq!(
        rows.iter()
            .map(|r| r["id"].as_u64().unwrap())
            .collect::<Vec<_>>(),
        [1, 2, 3, 4, 5, 6, 7],
        "{st}"
    );
    assert!(rows.iter().all(|r| r["position_deg"].is_f64()), "{st}");
    let joint2 = f(&rows[1]["position_deg"]);

    // Move joint 1 to 12° in position mode; status reads it there.
    assert_eq!(
        whj(&["mode", "1", "position"])["results"][0]["mode"],
        "position"
    );
    assert_eq!(whj(&["enable", "1"])["results"][0]["enabled"], true);
    let mv = whj(&["move", "1", "12", "--max-speed", "60"]);
    assert!(
        (f(&mv["results"][0]["position_deg"]) - 12.0).abs() <= 0.1,
        "{mv}"
    );
    let st = whj(&["status", "1-2"]);
    assert!(
        (f(&st["results"][0]["position_deg"]) - 12.0).abs() <= 0.2,
        "{st}"
    );
    assert!(
        (f(&st["results"][1]["position_deg"]) - joint2).abs() <= 0.2,
        "joint 2 moved: {st}"
    );
    assert_eq!(whj(&["disable", "1"])["results"][0]["enabled"], false);
}
