//! Helpers shared by the CLI tests: run the built `robobus` binary.

#![allow(dead_code)] // each test file uses a different subset
#![allow(clippy::unwrap_used, clippy::panic)] // test helpers: a failed unwrap is a failed test

use std::io::{BufRead as _, BufReader, Read as _};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::time::{Duration, Instant};

/// The result of one run.
#[derive(Debug)]
pub(crate) struct Run {
    /// Exit code (`None` if killed by a signal).
    pub(crate) code: Option<i32>,
    /// Standard output.
    pub(crate) stdout: String,
    /// Standard error.
    pub(crate) stderr: String,
}

impl From<Output> for Run {
    fn from(o: Output) -> Self {
        Self {
            code: o.status.code(),
            stdout: String::from_utf8_lossy(&o.stdout).into_owned(),
            stderr: String::from_utf8_lossy(&o.stderr).into_owned(),
        }
    }
}

/// Runs `robobus ARGS` with a clean logging environment.
pub(crate) fn robobus(args: &[&str]) -> Run {
    Command::new(env!("CARGO_BIN_EXE_robobus"))
        .args(args)
        .env_remove("RUST_LOG")
        .env("COLUMNS", "100")
        .stdin(Stdio::null())
        .output()
        .expect("robobus runs")
        .into()
}

/// Runs `robobus ARGS` and requires exit code 0; returns stdout.
#[track_caller]
pub(crate) fn ok(args: &[&str]) -> String {
    let r = robobus(args);
    assert_eq!(r.code, Some(0), "robobus {args:?} failed: {r:#?}");
    r.stdout
}

/// The non-comment lines of a dry-run's text output.
pub(crate) fn lines(stdout: &str) -> Vec<&str> {
    stdout
        .lines()
        .filter(|l| !l.starts_with('#') && !l.is_empty())
        .collect()
}

/// The lines of `stdout` as JSON values (`--json` outputs of one object per line).
#[track_caller]
pub(crate) fn json_lines(stdout: &str) -> Vec<serde_json::Value> {
    stdout
        .lines()
        .map(|l| serde_json::from_str(l).unwrap_or_else(|e| panic!("{e}: {l}")))
        .collect()
}

/// `robobus sim wck` in its own process on a pty symlink in a temporary directory, stopped
/// (SIGTERM) on drop.
pub(crate) struct WckSim {
    child: Child,
    link: PathBuf,
    _dir: tempfile::TempDir,
}

impl WckSim {
    /// Starts a simulated bus with `servos` (e.g. `0-2`) and waits until it is up.
    pub(crate) fn start(servos: &str, extra: &[&str]) -> Self {
        let dir = tempfile::tempdir().unwrap();
        let link = dir.path().join("wck");
        let mut child = Command::new(env!("CARGO_BIN_EXE_robobus"))
            .args(["sim", "wck", "--servos", servos, "--eeprom-ms", "5"])
            .args(extra)
            .arg("--link")
            .arg(&link)
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .unwrap();
        let mut first = String::new();
        BufReader::new(child.stdout.take().unwrap())
            .read_line(&mut first)
            .unwrap();
        assert_eq!(
            Path::new(first.trim()),
            link,
            "the sim prints the path first"
        );
        // Past the 65 ms a wCK module is deaf after power-up.
        std::thread::sleep(Duration::from_millis(120));
        Self {
            child,
            link,
            _dir: dir,
        }
    }

    /// The path clients open.
    pub(crate) fn port(&self) -> &str {
        self.link.to_str().unwrap()
    }

    /// Sends SIGINT and returns how long the simulator took to exit (at most `limit`).
    pub(crate) fn interrupt(&mut self, limit: Duration) -> Duration {
        let start = Instant::now();
        let _ = Command::new("kill")
            .arg("-INT")
            .arg(self.child.id().to_string())
            .status();
        while start.elapsed() < limit {
            if let Ok(Some(_)) = self.child.try_wait() {
                break;
            }
            std::thread::sleep(Duration::from_millis(10));
        }
        start.elapsed()
    }
}

/// Ends a simulator process with SIGTERM (the command's one handler leaves
/// devices and files in order), killing it only if it has not ended within 5 s.
pub(crate) fn terminate(child: &mut Child) {
    let _ = Command::new("kill")
        .arg("-TERM")
        .arg(child.id().to_string())
        .status();
    let deadline = Instant::now() + Duration::from_secs(5);
    while Instant::now() < deadline {
        if let Ok(Some(_)) = child.try_wait() {
            return;
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    let _ = child.kill();
    let _ = child.wait();
}

impl Drop for WckSim {
    fn drop(&mut self) {
        terminate(&mut self.child);
    }
}

/// `robobus sim whj --joints 1-7` (seed 3) on a UDP bus, up once it says it serves; killed
/// on drop.
pub(crate) struct WhjSim {
    child: Child,
    /// The bus address clients use.
    pub(crate) bus: String,
}

impl WhjSim {
    /// WHJ30 joints on `bus` (`udp:GROUP:PORT`), with the simulator's `extra` options.
    pub(crate) fn start(bus: &str, extra: &[&str]) -> Self {
        Self::start_model(bus, "whj30", extra)
    }

    /// [`WhjSim::start`] with joints of `model`.
    pub(crate) fn start_model(bus: &str, model: &str, extra: &[&str]) -> Self {
        let mut child = Command::new(env!("CARGO_BIN_EXE_robobus"))
            .args(["sim", "whj", "--joints", "1-7", "--model", model])
            .args(["--seed", "3"])
            .args(["--bus", bus])
            .args(extra)
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .expect("starting robobus sim whj");
        // Wait for its "serving" line.
        let mut err = child.stderr.take().unwrap();
        let start = Instant::now();
        let mut seen = Vec::new();
        let mut buf = [0u8; 256];
        while !String::from_utf8_lossy(&seen).contains("serving") {
            assert!(
                start.elapsed() < Duration::from_secs(20),
                "simulator did not start: {}",
                String::from_utf8_lossy(&seen)
            );
            let n = err.read(&mut buf).unwrap();
            assert!(
                n > 0,
                "simulator exited: {}",
                String::from_utf8_lossy(&seen)
            );
            seen.extend_from_slice(&buf[..n]);
        }
        // Keep draining stderr so the simulator never blocks on a full pipe.
        std::thread::spawn(move || std::io::copy(&mut err, &mut std::io::sink()));
        Self {
            child,
            bus: bus.to_owned(),
        }
    }

    /// `robobus whj --bus BUS ARGS`.
    pub(crate) fn whj(&self, args: &[&str]) -> Run {
        let mut all = vec!["whj", "--bus", self.bus.as_str()];
        all.extend_from_slice(args);
        robobus(&all)
    }

    /// `robobus whj --bus BUS --json ARGS`, expecting success; the `results` array.
    pub(crate) fn json(&self, args: &[&str]) -> Vec<serde_json::Value> {
        let mut all = vec!["--json"];
        all.extend_from_slice(args);
        let r = self.whj(&all);
        assert_eq!(r.code, Some(0), "whj {args:?} failed: {}", r.stderr);
        let doc: serde_json::Value = serde_json::from_str(&r.stdout)
            .unwrap_or_else(|e| panic!("whj {args:?}: not JSON ({e}): {}", r.stdout));
        assert_eq!(doc["bus"], self.bus.as_str());
        doc["results"].as_array().unwrap().clone()
    }
}

impl Drop for WhjSim {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}
