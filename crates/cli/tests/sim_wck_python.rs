//! Drives `robobus sim wck` from a separate Python process with pyserial and checks the
//! replies byte for byte (`scripts/py/wck_endpoint_check.py`). The test installs pyserial
//! into the shared venv (`target/pyenv`) with `scripts/py/ensure-pyserial`.

#![cfg(unix)] // the simulator on a pty, stopped with kill
#![allow(clippy::unwrap_used)] // test helpers

use std::io::{BufRead as _, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use robobus_testkit::workspace_root as workspace;

fn python() -> PathBuf {
    let out = Command::new(workspace().join("scripts/py/ensure-pyserial"))
        .stderr(Stdio::inherit())
        .output()
        .expect("running scripts/py/ensure-pyserial");
    assert!(out.status.success(), "ensure-pyserial failed: {out:?}");
    PathBuf::from(String::from_utf8(out.stdout).unwrap().trim())
}

#[test]
fn python_pyserial_client_gets_byte_exact_replies() {
    let py = python();
    let dir = tempfile::tempdir().unwrap();
    let link = dir.path().join("wck0");
    let mut sim = Command::new(env!("CARGO_BIN_EXE_robobus"))
        .args([
            "sim", "wck", "--servos", "0-5", "--model", "1108", "--baud", "115200",
        ])
        .arg("--link")
        .arg(&link)
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit())
        .spawn()
        .unwrap();
    let mut first_line = String::new();
    BufReader::new(sim.stdout.take().unwrap())
        .read_line(&mut first_line)
        .unwrap();
    assert_eq!(
        Path::new(first_line.trim()),
        link,
        "the first stdout line is the path to open"
    );
    assert!(
        std::fs::symlink_metadata(&link)
            .unwrap()
            .file_type()
            .is_symlink()
    );

    let python_run = Command::new(&py)
        .arg(workspace().join("scripts/py/wck_endpoint_check.py"))
        .arg(&link)
        .output()
        .unwrap();
    let report = String::from_utf8_lossy(&python_run.stdout);
    println!("{report}");

    // SIGTERM stops it cleanly and removes the symlink.
    let killed = Command::new("kill")
        .arg("-TERM")
        .arg(sim.id().to_string())
        .status()
        .unwrap();
    assert!(killed.success());
    let deadline = Instant::now() + Duration::from_secs(10);
    let status = loop {
        if let Some(s) = sim.try_wait().unwrap() {
            break s;
        }
        assert!(
            Instant::now() < deadline,
            "robobus sim wck did not stop on SIGTERM"
        );
        std::thread::sleep(Duration::from_millis(20));
    };
    assert!(
        python_run.status.success(),
        "python checks failed:\n{report}\n{}",
        String::from_utf8_lossy(&python_run.stderr)
    );
    assert!(report.contains("OK (0 failures)"), "{report}");
    assert!(status.success(), "{status:?}");
    assert!(
        std::fs::symlink_metadata(&link).is_err(),
        "symlink left behind"
    );
}
