//! `-v` logging: plain text (no ANSI escape codes) when stderr is not a terminal.

#![allow(clippy::unwrap_used, clippy::panic)] // test helpers: a failed unwrap is a failed test

use std::process::{Command, Stdio};

#[test]
fn verbose_logs_to_a_pipe_carry_no_escape_codes() {
    let out = Command::new(env!("CARGO_BIN_EXE_robobus"))
        .args(["-vv", "completions", "bash"])
        .env_remove("RUST_LOG")
        .env_remove("NO_COLOR")
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .output()
        .unwrap();
    assert!(out.status.success(), "{out:?}");
    let stderr = String::from_utf8_lossy(&out.stderr);
    // The log line is there (so the check below is not vacuous) ...
    assert!(
        stderr.contains("DEBUG") && stderr.contains("robobus logging"),
        "{stderr}"
    );
    // ... and it is plain text.
    assert!(
        !out.stderr.contains(&0x1b),
        "ESC byte in piped stderr: {stderr:?}"
    );
}
